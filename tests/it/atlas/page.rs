//! Pages put together from packed entries: every entry's texels where the table says, turned
//! entries included; padding the clamp of the entry's own edge; trim of transparent borders.

use cirrus::kinds::atlas::page::{composite_page, crop, opaque_bounds, page_texel, TrimRect};
use cirrus::packing::max_rects::{pack_pages, PageSettings};
use cirrus::texture::Texture;

/// A texture whose every texel differs from its neighbours and from other textures' (`seed`).
fn noise(width: u32, height: u32, seed: u32) -> Texture {
    let pixels = (0..width * height * 4)
        .map(|byte| ((byte.wrapping_mul(2654435761) ^ seed.wrapping_mul(40503)) >> 7) as u8 | 1)
        .collect();
    Texture::new(width, height, pixels)
}

#[test]
fn every_entry_reads_back_from_its_place_and_its_padding_repeats_its_own_edge() {
    // Long thin entries make the packer turn some of them.
    let textures: Vec<Texture> = [(40, 8), (8, 40), (33, 17), (5, 61), (64, 64), (3, 3), (90, 6), (12, 30)]
        .iter()
        .enumerate()
        .map(|(index, &(width, height))| noise(width, height, index as u32))
        .collect();
    let sizes: Vec<(u32, u32)> = textures.iter().map(|texture| (texture.width, texture.height)).collect();
    let padding = 4;
    let packing =
        pack_pages(&sizes, &PageSettings { max_size: 512, padding, rotate: true, power_of_two: false, pages: 1 })
            .unwrap();
    assert!(packing.placements.iter().any(|place| place.placement.rotated), "some entry is turned");
    let (width, height) = packing.pages[0];
    let entries: Vec<(&Texture, _)> =
        textures.iter().zip(&packing.placements).map(|(texture, place)| (texture, place.placement)).collect();
    let page = composite_page(width, height, &entries, padding);
    for (texture, placement) in &entries {
        for row in 0..texture.height {
            for column in 0..texture.width {
                let (x, y) = page_texel(placement, column, row);
                assert_eq!(page.texel(x, y), texture.texel(column, row), "{placement:?} texel ({column}, {row})");
            }
        }
        // The padding: beyond each corner and each edge, the entry's own nearest edge texel.
        let (span_x, span_y) =
            if placement.rotated { (placement.height, placement.width) } else { (placement.width, placement.height) };
        let (right, bottom) = (placement.x + span_x - 1, placement.y + span_y - 1);
        for step in 1..=padding {
            assert_eq!(page.texel(placement.x - step, placement.y - step), page.texel(placement.x, placement.y));
            assert_eq!(page.texel(right + step, bottom + step), page.texel(right, bottom));
            assert_eq!(page.texel(placement.x - step, bottom), page.texel(placement.x, bottom));
            assert_eq!(page.texel(right, placement.y - step), page.texel(right, placement.y));
        }
    }
    // No texel outside the entries and their padding is a colour none of them has, and there
    // alpha is 0 (these entries have transparency).
    let mut known: std::collections::HashSet<[u8; 3]> = std::collections::HashSet::new();
    for texture in &textures {
        known.extend(texture.pixels.chunks_exact(4).map(|texel| <[u8; 3]>::try_from(&texel[..3]).unwrap()));
    }
    assert!(page.pixels.chunks_exact(4).all(|texel| known.contains(&texel[..3])), "the fill copies entry colours only");
    assert_eq!(page.texel(width - 1, height - 1)[3], 0, "the page's far corner is fill, transparent");
}

#[test]
fn trim_keeps_the_smallest_rectangle_with_any_alpha_and_where_it_was() {
    let mut pixels = vec![0u8; 10 * 8 * 4];
    for (x, y) in [(3, 2), (6, 5), (4, 4)] {
        pixels[(y * 10 + x) * 4..][..4].copy_from_slice(&[200, 100, 50, 1]);
    }
    let sprite = Texture::new(10, 8, pixels);
    let bounds = opaque_bounds(&sprite);
    assert_eq!(bounds, TrimRect { x: 3, y: 2, width: 4, height: 4 });
    let kept = crop(&sprite, bounds);
    assert_eq!((kept.width, kept.height), (4, 4));
    assert_eq!(kept.texel(0, 0), [200, 100, 50, 1]);
    assert_eq!(kept.texel(3, 3), [200, 100, 50, 1]);
    assert_eq!(kept.texel(1, 2), [200, 100, 50, 1]);
    // Nothing visible: the entry keeps one texel.
    assert_eq!(opaque_bounds(&Texture::constant(5, 5, [9, 9, 9, 0])), TrimRect { x: 0, y: 0, width: 1, height: 1 });
    // Opaque: nothing to trim, and the crop is the texture itself.
    let opaque = Texture::constant(6, 3, [1, 2, 3, 255]);
    assert_eq!(crop(&opaque, opaque_bounds(&opaque)), opaque);
}

#[test]
fn a_source_uv_through_the_table_lands_on_the_page_texel_of_that_source_texel() {
    use cirrus::kinds::atlas::table::{AtlasEntry, UvTransform};
    // Sprites with transparent borders (trimmed), some long enough to be turned.
    let sprites: Vec<Texture> = [(40, 12, 3), (12, 50, 5), (30, 30, 0), (64, 9, 2), (7, 33, 1)]
        .iter()
        .enumerate()
        .map(|(index, &(width, height, border))| {
            let inner = noise(width - 2 * border, height - 2 * border, index as u32 + 10);
            let mut pixels = vec![0u8; (width * height * 4) as usize];
            for y in 0..inner.height {
                for x in 0..inner.width {
                    let at = (((y + border) * width + x + border) * 4) as usize;
                    pixels[at..at + 4].copy_from_slice(&inner.texel(x, y));
                }
            }
            Texture::new(width, height, pixels)
        })
        .collect();
    let trims: Vec<TrimRect> = sprites.iter().map(opaque_bounds).collect();
    let kept: Vec<Texture> = sprites.iter().zip(&trims).map(|(sprite, &trim)| crop(sprite, trim)).collect();
    // Placed by hand, every other one turned, one after the other along the page.
    let (page_width, page_height) = (256, 128);
    let mut x = 4;
    let placements: Vec<cirrus::packing::Placement> = kept
        .iter()
        .enumerate()
        .map(|(index, texture)| {
            let rotated = index % 2 == 1;
            let placement =
                cirrus::packing::Placement { x, y: 4, width: texture.width, height: texture.height, rotated };
            x += if rotated { texture.height } else { texture.width } + 8;
            placement
        })
        .collect();
    let entries: Vec<(&Texture, _)> =
        kept.iter().zip(&placements).map(|(texture, &placement)| (texture, placement)).collect();
    let page = composite_page(page_width, page_height, &entries, 2);
    for ((sprite, trim), placement) in sprites.iter().zip(&trims).zip(&placements) {
        let source_size = [sprite.width, sprite.height];
        let UvTransform { uv_offset, uv_scale, .. } =
            UvTransform::of(placement, *trim, source_size, (page_width, page_height));
        let entry = AtlasEntry {
            name: String::new(),
            page: 0,
            x: placement.x,
            y: placement.y,
            width: trim.width,
            height: trim.height,
            rotated: placement.rotated,
            source_size,
            trim_offset: [trim.x, trim.y],
            uv_offset,
            uv_scale,
            aliases: Vec::new(),
        };
        for row in trim.y..trim.y + trim.height {
            for column in trim.x..trim.x + trim.width {
                // The texel's centre as a UV of the source (v up).
                let uv = [(column as f64 + 0.5) / sprite.width as f64, 1.0 - (row as f64 + 0.5) / sprite.height as f64];
                let [u, v] = entry.page_uv(uv);
                let (x, y) = ((u * page_width as f64).floor() as u32, ((1.0 - v) * page_height as f64).floor() as u32);
                assert_eq!(
                    (x, y),
                    page_texel(placement, column - trim.x, row - trim.y),
                    "{entry:?} texel ({column}, {row})"
                );
                assert_eq!(page.texel(x, y), sprite.texel(column, row));
            }
        }
    }
}

#[test]
fn a_page_recomposited_from_its_last_composite_equals_one_composited_afresh() {
    use cirrus::kinds::atlas::page::{composite_page_keeping_sources, recomposite_page, PageEntry};
    let mut textures: Vec<Texture> = [(40, 8), (8, 40), (33, 17), (64, 64), (3, 3)]
        .iter()
        .enumerate()
        .map(|(index, &(w, h))| noise(w, h, index as u32))
        .collect();
    let sizes: Vec<(u32, u32)> = textures.iter().map(|texture| (texture.width, texture.height)).collect();
    let padding = 3;
    let packing =
        pack_pages(&sizes, &PageSettings { max_size: 256, padding, rotate: true, power_of_two: false, pages: 1 })
            .unwrap();
    let (width, height) = packing.pages[0];
    let entries = |textures: &[Texture]| -> Vec<PageEntry> {
        textures
            .iter()
            .zip(&packing.placements)
            .map(|(texture, place)| PageEntry {
                placement: place.placement,
                kept_hash: *texture.hash.as_bytes(),
                translucent: true,
            })
            .collect()
    };
    let with_places = |textures: &[Texture]| -> Vec<(Texture, _)> {
        textures.iter().cloned().zip(packing.placements.iter().map(|p| p.placement)).collect()
    };
    let before = with_places(&textures);
    let before: Vec<(&Texture, _)> = before.iter().map(|(texture, placement)| (texture, *placement)).collect();
    let (first, sources) = composite_page_keeping_sources(width, height, &before, padding);
    // Two entries repainted, one of them turned on the page if any is.
    let turned = packing.placements.iter().position(|place| place.placement.rotated).unwrap_or(1);
    for index in [turned, 3] {
        textures[index] = noise(textures[index].width, textures[index].height, 100 + index as u32);
    }
    let after = with_places(&textures);
    let after: Vec<(&Texture, _)> = after.iter().map(|(texture, placement)| (texture, *placement)).collect();
    let (fresh, _) = composite_page_keeping_sources(width, height, &after, padding);
    let changed = [(turned, &textures[turned]), (3, &textures[3])];
    let again = recomposite_page(&first, &sources, &entries(&textures), &changed, padding);
    assert_ne!(first.hash, fresh.hash, "the edit changed the page");
    assert!(again.pixels == fresh.pixels, "recomposited page differs from a fresh composite");
}
