//! Mip chains: each level an area-weighted reduction of the one above, with the filtering each
//! surface needs (colour in linear light and alpha-weighted, coverage-preserving alpha for
//! alpha-tested albedo, renormalised normals, plain averages for data).

use rayon::prelude::*;

use crate::color::{
    decode_normal, encode_normal, linear_to_srgb_u8, normalize_tangent_normal, srgb_u8_to_linear, unorm_u8,
};
use crate::fingerprint::BlockFingerprints;
use crate::SurfaceKind;
use crate::Texture;

/// How the levels of one surface are filtered.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MipSettings {
    pub kind: SurfaceKind,
    /// Alpha-tested albedo: keep the fraction of texels above this cutoff equal on every level.
    pub alpha_cutoff: Option<f32>,
}

/// Level 0 followed by every smaller level down to 1×1.
pub fn mip_chain(level0: &Texture, settings: MipSettings) -> Vec<Texture> {
    full_chain(level0, settings, usize::MAX).0
}

/// Level `halvings` of [`mip_chain`] (level 0 itself for 0): a surface stored at a fraction of
/// the size it was made at, filtered as its lower levels would be.
pub fn reduced_level(level0: &Texture, settings: MipSettings, halvings: u32) -> Texture {
    if halvings == 0 {
        return level0.clone();
    }
    // The chain down to that level only: each level's alpha scale is sought from level 0's
    // coverage alone, so the levels above are those of the whole chain.
    let mut chain = full_chain(level0, settings, halvings as usize + 1).0;
    chain.pop().expect("level 0")
}

/// `level0` stored `factor` times smaller a side (its sides multiples of `factor`):
/// [`reduced_level`] where `factor` is a power of two, else one box filter of `factor`² texels in
/// the space a chain filters in, level 0's alpha-tested coverage kept as a chain's levels keep
/// it (an impostor's frames reduced from a render at five times their size).
pub fn reduced_by(level0: &Texture, settings: MipSettings, factor: u32) -> Texture {
    let factor = factor.max(1);
    if factor.is_power_of_two() {
        return reduced_level(level0, settings, factor.ilog2());
    }
    let to = ((level0.width / factor).max(1), (level0.height / factor).max(1));
    let (current, straight) = level0_texels(level0, settings);
    let coverage = level_coverage(level0, settings);
    reduced_texels(&current, straight.as_ref(), (level0.width, level0.height), to, settings, coverage).level
}

/// Level 0's texels as a chain's first reduction reads them, and their straight colour where a
/// chain keeps it.
fn level0_texels(level0: &Texture, settings: MipSettings) -> (Texels<'_>, Option<Texels<'_>>) {
    // Reduce from unscaled float levels so that coverage scaling does not compound. Level 0's
    // bytes are converted to filter space as the first reduction reads them (four 2048² surfaces
    // would otherwise each allocate, fault in and fill 64 MiB of floats for one pass).
    let current = Texels::Level0(&level0.pixels, filter_space_of(settings.kind));
    // Straight (not alpha-weighted) linear colour, for albedo texels whose whole footprint is
    // transparent: alpha weighting would leave them black, and bilinear filtering at an
    // alpha-tested edge would then pull the visible colour toward black.
    let straight = keeps_straight_colour(level0, settings)
        .then_some(Texels::Level0(&level0.pixels, straight_linear_texel as FilterTexel));
    (current, straight)
}

/// The share of `level0`'s texels that pass its alpha test (`None`: it has none).
fn level_coverage(level0: &Texture, settings: MipSettings) -> Option<f32> {
    let to_filter = filter_space_of(settings.kind);
    settings.alpha_cutoff.map(|cutoff| {
        let passing = level0.pixels.par_chunks_exact(4).filter(|texel| to_filter(texel)[3] > cutoff).count();
        passing as f32 / (level0.pixels.len() / 4).max(1) as f32
    })
}

/// The alpha scale that gives the `reduced` texels of a level level 0's `coverage` at the
/// alpha test (1: no test, or all or nothing passes on level 0, and so on every level).
fn coverage_keeping_scale(reduced: &[[f32; 4]], settings: MipSettings, coverage: Option<f32>) -> f32 {
    match (settings.alpha_cutoff, coverage) {
        (Some(_), Some(coverage)) if coverage == 0.0 || coverage == 1.0 => 1.0,
        (Some(cutoff), Some(coverage)) => coverage_alpha_scale(reduced, cutoff, coverage),
        _ => 1.0,
    }
}

/// Side of the tiles that [`mip_chain_reusing`] filters again on their own: with sizes that are
/// multiples of it, each of the first `REUSE_TILE_LEVELS` levels reduces within the tile.
const REUSE_TILE: usize = 64;
const REUSE_TILE_LEVELS: usize = 6;

/// What a mip chain keeps so that the next chain of the same surface can filter only the tiles
/// that changed: the filter-space texels of the level with one texel per tile, and the alpha
/// scale of every level.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct MipReuse {
    settings: MipSettings,
    coverage: Option<f32>,
    alpha_scales: Vec<f32>,
    tile_level: TileLevel,
}

/// The filter-space texels of the level with one texel per tile, and their straight colour.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
struct TileLevel {
    texels: Vec<[f32; 4]>,
    straight: Option<Vec<[f32; 4]>>,
}

/// What [`mip_chain_reusing`] reuses of the chain made before for the same surface: the block
/// fingerprints of its level 0 (not the level itself: it is the largest, and only which tiles
/// changed matters), its other levels, and what it kept for reuse.
#[derive(Clone, Copy, Debug)]
pub struct PreviousChain<'a> {
    pub level0_blocks: &'a BlockFingerprints,
    pub lower_levels: &'a [Texture],
    pub reuse: &'a MipReuse,
}

/// Like [`mip_chain`], reusing `previous`: when only colour changed (alpha identical), only the
/// 64² tiles of level 0 that changed (by `level0_blocks`, the fingerprints of `level0`) are
/// filtered again, and the coarse levels from one texel per tile. The levels are identical to a
/// full chain's; the [`MipReuse`] is for the next call (none for sizes that are not multiples
/// of the tile).
pub fn mip_chain_reusing(
    level0: &Texture,
    level0_blocks: &BlockFingerprints,
    settings: MipSettings,
    previous: Option<PreviousChain>,
) -> (Vec<Texture>, Option<MipReuse>) {
    previous
        .and_then(|previous| refilter_changed_tiles(level0, level0_blocks, settings, previous))
        .unwrap_or_else(|| full_chain(level0, settings, usize::MAX))
}

fn reusable_size(width: u32, height: u32) -> bool {
    (width as usize).is_multiple_of(REUSE_TILE) && (height as usize).is_multiple_of(REUSE_TILE)
}

/// Level 0 and the levels below it, `max_levels` at most, and what a next chain may reuse.
fn full_chain(level0: &Texture, settings: MipSettings, max_levels: usize) -> (Vec<Texture>, Option<MipReuse>) {
    let (current, straight) = level0_texels(level0, settings);
    let coverage = level_coverage(level0, settings);
    let mut chain = Chain { levels: vec![level0.clone()], alpha_scales: vec![1.0], tile_level: None, max_levels };
    let keep_tile_level = reusable_size(level0.width, level0.height);
    extend_chain(&mut chain, current, straight, settings, coverage, keep_tile_level);
    let reuse = chain.tile_level.map(|tile_level| MipReuse {
        settings,
        coverage,
        alpha_scales: chain.alpha_scales,
        tile_level,
    });
    (chain.levels, reuse)
}

/// Whether a chain keeps straight colour beside the alpha-weighted one: albedo with some fully
/// transparent texel.
fn keeps_straight_colour(level0: &Texture, settings: MipSettings) -> bool {
    settings.kind == SurfaceKind::Albedo && level0.pixels.par_chunks_exact(4).any(|texel| texel[3] == 0)
}

/// Levels made so far, the alpha scale of each, the tile level's texels once reached, and how
/// many levels the chain stops at (down to 1×1 at most).
struct Chain {
    levels: Vec<Texture>,
    alpha_scales: Vec<f32>,
    tile_level: Option<TileLevel>,
    max_levels: usize,
}

/// The sizes of a full mip chain of a `width` × `height` level 0, level 0 first: each level
/// halves (rounding down, at least 1) down to 1 × 1, as [`extend_chain`] makes them.
pub fn chain_sizes(width: u32, height: u32) -> Vec<(u32, u32)> {
    let mut sizes = vec![(width, height)];
    let (mut width, mut height) = (width, height);
    while width > 1 || height > 1 {
        (width, height) = next_level_size(width, height);
        sizes.push((width, height));
    }
    sizes
}

/// The size of the level below a `width` × `height` one: halved, rounding down, at least 1.
fn next_level_size(width: u32, height: u32) -> (u32, u32) {
    ((width / 2).max(1), (height / 2).max(1))
}

/// Reduces `current` (the filter-space texels of the chain's last level) level by level down to
/// 1×1 (or the chain's `max_levels`), appending each level and its alpha scale.
fn extend_chain(
    chain: &mut Chain,
    mut current: Texels,
    mut straight: Option<Texels>,
    settings: MipSettings,
    coverage: Option<f32>,
    keep_tile_level: bool,
) {
    let last = chain.levels.last().expect("level 0");
    let (mut width, mut height) = (last.width, last.height);
    while (width > 1 || height > 1) && chain.levels.len() < chain.max_levels {
        let next = next_level_size(width, height);
        let ReducedLevel { level, texels: reduced, straight: reduced_straight, alpha_scale } =
            reduced_texels(&current, straight.as_ref(), (width, height), next, settings, coverage);
        (width, height) = next;
        chain.levels.push(level);
        chain.alpha_scales.push(alpha_scale);
        if keep_tile_level && chain.levels.len() == REUSE_TILE_LEVELS + 1 {
            chain.tile_level = Some(TileLevel { texels: reduced.clone(), straight: reduced_straight.clone() });
        }
        current = Texels::Stored(reduced);
        straight = reduced_straight.map(Texels::Stored);
    }
}

/// A level made from the one above it, and what the next level reduces.
struct ReducedLevel {
    level: Texture,
    /// Its filter-space texels (before the alpha scale) and straight colour, where kept.
    texels: Vec<[f32; 4]>,
    straight: Option<Vec<[f32; 4]>>,
    alpha_scale: f32,
}

/// `current` (`from` texels, with their `straight` colour where kept) reduced to `to` texels,
/// with level 0's `coverage` kept at the alpha test.
fn reduced_texels(
    current: &Texels,
    straight: Option<&Texels>,
    (width, height): (u32, u32),
    (new_width, new_height): (u32, u32),
    settings: MipSettings,
    coverage: Option<f32>,
) -> ReducedLevel {
    let texels = current.reduce(width, height, new_width, new_height);
    let straight = straight.map(|colour| colour.reduce(width, height, new_width, new_height));
    let alpha_scale = coverage_keeping_scale(&texels, settings, coverage);
    let level = from_filter_space(&texels, straight.as_deref(), new_width, new_height, settings.kind, alpha_scale);
    ReducedLevel { level, texels, straight, alpha_scale }
}

/// A level's texels in filter space: stored, or level 0's RGBA8 bytes converted as they are read.
enum Texels<'a> {
    Stored(Vec<[f32; 4]>),
    Level0(&'a [u8], FilterTexel),
}

/// One RGBA8 texel in filter space.
type FilterTexel = fn(&[u8]) -> [f32; 4];

impl Texels<'_> {
    /// [`reduce`] of these `width` × `height` texels.
    fn reduce(&self, width: u32, height: u32, new_width: u32, new_height: u32) -> Vec<[f32; 4]> {
        match self {
            Texels::Stored(texels) => reduce(texels, width, height, new_width, new_height),
            Texels::Level0(pixels, convert) if width == 2 * new_width && height == 2 * new_height => halve(
                |index| convert(&pixels[index * 4..][..4]),
                width as usize,
                new_width as usize,
                new_height as usize,
            ),
            Texels::Level0(pixels, convert) => {
                let texels: Vec<[f32; 4]> = pixels.par_chunks_exact(4).map(convert).collect();
                reduce(&texels, width, height, new_width, new_height)
            }
        }
    }
}

/// The incremental path of [`mip_chain_reusing`]; `None` when it does not apply (other settings
/// or size, or alpha changed: alpha moves the coverage scale of whole levels).
fn refilter_changed_tiles(
    level0: &Texture,
    level0_blocks: &BlockFingerprints,
    settings: MipSettings,
    previous: PreviousChain,
) -> Option<(Vec<Texture>, Option<MipReuse>)> {
    let (width, height) = (level0.width, level0.height);
    if previous.reuse.settings != settings
        || (level0_blocks.width, level0_blocks.height) != (width, height)
        || !level0_blocks.same_size(previous.level0_blocks)
        || !reusable_size(width, height)
        || previous.lower_levels.len() + 1 != previous.reuse.alpha_scales.len()
    {
        return None;
    }
    let (tiles_x, tiles_y) = (width as usize / REUSE_TILE, height as usize / REUSE_TILE);
    let row_bytes = width as usize * 4;
    let tile_rows = |tile: usize| {
        let (x, y) = (tile % tiles_x * REUSE_TILE, tile / tiles_x * REUSE_TILE);
        (y..y + REUSE_TILE).map(move |row| row * row_bytes + x * 4..row * row_bytes + (x + REUSE_TILE) * 4)
    };
    // Per tile: whether any of its blocks changed, and whether any alpha did.
    let (tile_blocks, blocks_x) = (REUSE_TILE / 4, level0_blocks.blocks_x());
    let changes: Vec<(bool, bool)> = (0..tiles_x * tiles_y)
        .into_par_iter()
        .map(|tile| {
            let (first_x, first_y) = (tile % tiles_x * tile_blocks, tile / tiles_x * tile_blocks);
            let mut changed = false;
            for by in first_y..first_y + tile_blocks {
                for number in by * blocks_x + first_x..by * blocks_x + first_x + tile_blocks {
                    if level0_blocks.block_changed(previous.level0_blocks, number) {
                        changed = true;
                        if level0_blocks.alpha_changed(previous.level0_blocks, number) {
                            return (true, true);
                        }
                    }
                }
            }
            (changed, false)
        })
        .collect();
    // An alpha edit under coverage preservation moves whole levels' alpha scale; without it,
    // alpha is filtered within the tile like colour, unless the edit decides whether any texel
    // is fully transparent (which decides whether straight colour is kept at all).
    let alpha_changed = changes.iter().any(|&(_, alpha_changed)| alpha_changed);
    if alpha_changed
        && (settings.alpha_cutoff.is_some()
            || keeps_straight_colour(level0, settings) != previous.reuse.tile_level.straight.is_some())
    {
        return None;
    }
    let changed_tiles: Vec<usize> =
        changes.iter().enumerate().filter(|(_, (changed, _))| *changed).map(|(tile, _)| tile).collect();
    // Each changed tile filtered on its own, with the arithmetic of a full chain: its bytes at
    // levels 1 to REUSE_TILE_LEVELS, and its one texel at the last of them.
    type Refiltered = (usize, Vec<Vec<u8>>, [f32; 4], Option<[f32; 4]>);
    let refiltered: Vec<Refiltered> = changed_tiles
        .par_iter()
        .map(|&tile| {
            let pixels: Vec<u8> = tile_rows(tile).flat_map(|range| level0.pixels[range].iter().copied()).collect();
            let mut current = to_filter_space(&pixels, settings.kind);
            let mut straight = previous.reuse.tile_level.straight.is_some().then(|| straight_linear_colour(&pixels));
            let mut side = REUSE_TILE as u32;
            let mut bytes = Vec::with_capacity(REUSE_TILE_LEVELS);
            for level in 1..=REUSE_TILE_LEVELS {
                current = reduce(&current, side, side, side / 2, side / 2);
                straight = straight.map(|colour| reduce(&colour, side, side, side / 2, side / 2));
                side /= 2;
                bytes.push(filter_space_bytes(
                    &current,
                    straight.as_deref(),
                    settings.kind,
                    previous.reuse.alpha_scales[level],
                ));
            }
            (tile, bytes, current[0], straight.map(|colour| colour[0]))
        })
        .collect();
    let mut levels = vec![level0.clone()];
    for level in 1..=REUSE_TILE_LEVELS {
        let mut pixels = previous.lower_levels[level - 1].pixels.to_vec();
        let (level_width, side) = (width as usize >> level, REUSE_TILE >> level);
        for (tile, bytes, _, _) in &refiltered {
            let (x, y) = (tile % tiles_x * side, tile / tiles_x * side);
            for (row, source) in bytes[level - 1].chunks_exact(side * 4).enumerate() {
                let start = ((y + row) * level_width + x) * 4;
                pixels[start..start + side * 4].copy_from_slice(source);
            }
        }
        levels.push(Texture::new(width >> level, height >> level, pixels));
    }
    let mut tile_level = previous.reuse.tile_level.clone();
    for (tile, _, texel, straight_texel) in &refiltered {
        tile_level.texels[*tile] = *texel;
        if let (Some(straight), Some(texel)) = (tile_level.straight.as_mut(), straight_texel) {
            straight[*tile] = *texel;
        }
    }
    let alpha_scales = previous.reuse.alpha_scales[..=REUSE_TILE_LEVELS].to_vec();
    let mut chain = Chain { levels, alpha_scales, tile_level: None, max_levels: usize::MAX };
    extend_chain(
        &mut chain,
        Texels::Stored(tile_level.texels.clone()),
        tile_level.straight.clone().map(Texels::Stored),
        settings,
        previous.reuse.coverage,
        false,
    );
    let reuse = MipReuse { settings, coverage: previous.reuse.coverage, alpha_scales: chain.alpha_scales, tile_level };
    Some((chain.levels, Some(reuse)))
}

/// Texels as floats in the space where averaging is right: linear premultiplied colour for
/// albedo, unit vectors for normals, plain values for data.
fn to_filter_space(pixels: &[u8], kind: SurfaceKind) -> Vec<[f32; 4]> {
    pixels.par_chunks_exact(4).map(filter_space_of(kind)).collect()
}

/// The conversion of one RGBA8 texel of a `kind` surface to filter space (see [`to_filter_space`]).
fn filter_space_of(kind: SurfaceKind) -> FilterTexel {
    match kind {
        SurfaceKind::Albedo => |t| {
            let alpha = t[3] as f32 / 255.0;
            [srgb_u8_to_linear(t[0]) * alpha, srgb_u8_to_linear(t[1]) * alpha, srgb_u8_to_linear(t[2]) * alpha, alpha]
        },
        SurfaceKind::Normal => |t| {
            let [x, y, z] = decode_normal([t[0], t[1], t[2]]);
            [x, y, z, 1.0]
        },
        SurfaceKind::Mra | SurfaceKind::Height | SurfaceKind::Ao => {
            |t| [t[0], t[1], t[2], t[3]].map(|c| c as f32 / 255.0)
        }
    }
}

/// Linear colour of every texel, not weighted by alpha.
fn straight_linear_colour(pixels: &[u8]) -> Vec<[f32; 4]> {
    pixels.par_chunks_exact(4).map(straight_linear_texel).collect()
}

/// Linear colour of one RGBA8 texel, not weighted by alpha.
fn straight_linear_texel(t: &[u8]) -> [f32; 4] {
    [srgb_u8_to_linear(t[0]), srgb_u8_to_linear(t[1]), srgb_u8_to_linear(t[2]), 1.0]
}

fn from_filter_space(
    texels: &[[f32; 4]],
    straight: Option<&[[f32; 4]]>,
    width: u32,
    height: u32,
    kind: SurfaceKind,
    alpha_scale: f32,
) -> Texture {
    // One loop per kind, so that the kind is no per-texel branch and the data kinds' loop is
    // plain arithmetic the compiler vectorises.
    let pixels = match kind {
        SurfaceKind::Albedo => texels_to_bytes(texels, straight, |texel, straight| {
            texel_bytes(texel, straight, SurfaceKind::Albedo, alpha_scale)
        }),
        SurfaceKind::Normal => {
            texels_to_bytes(texels, None, |texel, _| texel_bytes(texel, None, SurfaceKind::Normal, alpha_scale))
        }
        SurfaceKind::Mra | SurfaceKind::Height | SurfaceKind::Ao => {
            texels_to_bytes(texels, None, |texel, _| texel_bytes(texel, None, SurfaceKind::Mra, alpha_scale))
        }
    };
    Texture::new(width, height, pixels)
}

/// `convert` of every texel (with its straight colour when there is one) into RGBA8 bytes.
fn texels_to_bytes(
    texels: &[[f32; 4]],
    straight: Option<&[[f32; 4]]>,
    convert: impl Fn([f32; 4], Option<[f32; 4]>) -> [u8; 4] + Sync,
) -> Vec<u8> {
    const CHUNK: usize = 4096;
    let mut pixels = vec![0u8; texels.len() * 4];
    pixels.par_chunks_mut(CHUNK * 4).enumerate().for_each(|(chunk, bytes)| {
        let texels = &texels[chunk * CHUNK..][..bytes.len() / 4];
        match straight {
            Some(straight) => {
                let straight = &straight[chunk * CHUNK..][..bytes.len() / 4];
                for ((bytes, &texel), &straight) in bytes.chunks_exact_mut(4).zip(texels).zip(straight) {
                    bytes.copy_from_slice(&convert(texel, Some(straight)));
                }
            }
            None => {
                for (bytes, &texel) in bytes.chunks_exact_mut(4).zip(texels) {
                    bytes.copy_from_slice(&convert(texel, None));
                }
            }
        }
    });
    pixels
}

/// [`from_filter_space`] of a few texels, on this thread.
fn filter_space_bytes(
    texels: &[[f32; 4]],
    straight: Option<&[[f32; 4]]>,
    kind: SurfaceKind,
    alpha_scale: f32,
) -> Vec<u8> {
    texels
        .iter()
        .enumerate()
        .flat_map(|(index, &texel)| texel_bytes(texel, straight.map(|straight| straight[index]), kind, alpha_scale))
        .collect()
}

#[inline(always)]
fn texel_bytes([r, g, b, a]: [f32; 4], straight: Option<[f32; 4]>, kind: SurfaceKind, alpha_scale: f32) -> [u8; 4] {
    match kind {
        SurfaceKind::Albedo => {
            // Un-premultiply; fully transparent texels take the plain average colour of their
            // footprint (the colour a fill extended there), not black.
            let (r, g, b) = match straight {
                _ if a > 1e-6 => (r / a, g / a, b / a),
                Some(straight) => (straight[0], straight[1], straight[2]),
                None => (r, g, b),
            };
            [linear_to_srgb_u8(r), linear_to_srgb_u8(g), linear_to_srgb_u8(b), unorm_u8(a * alpha_scale)]
        }
        SurfaceKind::Normal => encode_normal(normalize_tangent_normal([r, g, b])),
        SurfaceKind::Mra | SurfaceKind::Height | SurfaceKind::Ao => {
            [unorm_u8(r), unorm_u8(g), unorm_u8(b), unorm_u8(a)]
        }
    }
}

/// Area-weighted box reduction (handles odd sizes: each target texel covers a fractional
/// footprint of the source).
fn reduce(source: &[[f32; 4]], width: u32, height: u32, new_width: u32, new_height: u32) -> Vec<[f32; 4]> {
    if width == 2 * new_width && height == 2 * new_height {
        return halve(|index| source[index], width as usize, new_width as usize, new_height as usize);
    }
    let scale_x = width as f32 / new_width as f32;
    let scale_y = height as f32 / new_height as f32;
    let weights = |index: u32, scale: f32, limit: u32| -> Vec<(u32, f32)> {
        let start = index as f32 * scale;
        let end = start + scale;
        let mut result = Vec::new();
        let mut texel = start.floor() as u32;
        while (texel as f32) < end && texel < limit {
            let overlap = (end.min(texel as f32 + 1.0) - start.max(texel as f32)).max(0.0);
            if overlap > 0.0 {
                result.push((texel, overlap / scale));
            }
            texel += 1;
        }
        result
    };
    let columns: Vec<Vec<(u32, f32)>> = (0..new_width).map(|x| weights(x, scale_x, width)).collect();
    // Rows in parallel: each output texel is the same arithmetic whichever thread computes it.
    (0..new_height)
        .into_par_iter()
        .flat_map_iter(|y| {
            let rows = weights(y, scale_y, height);
            columns
                .iter()
                .map(|column| {
                    let mut sum = [0.0f32; 4];
                    for &(sy, wy) in &rows {
                        for &(sx, wx) in column {
                            let texel = source[(sy * width + sx) as usize];
                            let weight = wx * wy;
                            for channel in 0..4 {
                                sum[channel] += texel[channel] * weight;
                            }
                        }
                    }
                    sum
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// [`reduce`] of a level with even sides to half its size: each texel is the sum of its four
/// source texels weighted by a quarter, added in the order the general reduction adds them (so
/// the sums are the same to the bit), without its per-texel weight lists.
fn halve(
    source: impl Fn(usize) -> [f32; 4] + Sync,
    width: usize,
    new_width: usize,
    new_height: usize,
) -> Vec<[f32; 4]> {
    let mut reduced = vec![[0.0f32; 4]; new_width * new_height];
    reduced.par_chunks_mut(new_width).enumerate().for_each(|(y, row)| {
        let (top, bottom) = (2 * y * width, (2 * y + 1) * width);
        for (x, texel) in row.iter_mut().enumerate() {
            let mut sum = [0.0f32; 4];
            for corner in [top + 2 * x, top + 2 * x + 1, bottom + 2 * x, bottom + 2 * x + 1].map(&source) {
                for channel in 0..4 {
                    sum[channel] += corner[channel] * 0.25;
                }
            }
            *texel = sum;
        }
    });
    reduced
}

/// Fraction of texels whose alpha × `scale` passes `cutoff`.
fn alpha_coverage(texels: &[[f32; 4]], cutoff: f32, scale: f32) -> f32 {
    let passing = texels.par_iter().filter(|texel| texel[3] * scale > cutoff).count();
    passing as f32 / texels.len().max(1) as f32
}

/// The alpha scale that makes this level's coverage closest to `target` (bisection).
fn coverage_alpha_scale(texels: &[[f32; 4]], cutoff: f32, target: f32) -> f32 {
    let (mut low, mut high) = (0.0f32, 4.0f32);
    for _ in 0..20 {
        let middle = 0.5 * (low + high);
        if alpha_coverage(texels, cutoff, middle) < target {
            low = middle;
        } else {
            high = middle;
        }
    }
    [low, high]
        .into_iter()
        .min_by(|a, b| {
            let error = |scale: f32| (alpha_coverage(texels, cutoff, scale) - target).abs();
            error(*a).total_cmp(&error(*b))
        })
        .unwrap_or(1.0)
}

/// Fraction of texels of an RGBA8 texture whose alpha passes `cutoff` (for tests and reports).
pub fn texture_alpha_coverage(texture: &Texture, cutoff: f32) -> f32 {
    let passing = texture.pixels.chunks_exact(4).filter(|texel| texel[3] as f32 / 255.0 > cutoff).count();
    passing as f32 / (texture.width * texture.height) as f32
}
