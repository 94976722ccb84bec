//! Block-compressed textures: every mip level encoded to BC1/BC3/BC4/BC5/BC7, by Intel's ISPC
//! texture compressor for BC1/BC3/BC7 (through `ispc`, at the process's ISA level) in parallel
//! strips of blocks, and by cirrus's own BC4 search (`bc4`) per block for BC4 and BC5.

use std::fmt;
use std::sync::Arc;

use rayon::prelude::*;

use crate::fingerprint::BlockFingerprints;
use crate::format::{BlockFormat, EncodeQuality};
use crate::Texture;
use base::stop::{never, ShouldStop, Stopped};

/// One texture, block-compressed, all levels. Equality is by content hash.
#[derive(Clone)]
pub struct EncodedTexture {
    pub format: BlockFormat,
    pub srgb: bool,
    pub width: u32,
    pub height: u32,
    /// Block data per level, level 0 first.
    pub levels: Vec<Arc<[u8]>>,
    pub hash: blake3::Hash,
}

impl PartialEq for EncodedTexture {
    fn eq(&self, other: &Self) -> bool {
        self.hash == other.hash && self.format == other.format && self.srgb == other.srgb
    }
}

impl Eq for EncodedTexture {}

impl fmt::Debug for EncodedTexture {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "EncodedTexture({:?} {}x{} ×{}, {})",
            self.format,
            self.width,
            self.height,
            self.levels.len(),
            &self.hash.to_hex()[..12]
        )
    }
}

/// Bits per texel of a format (a block's bits over its 16 texels).
pub fn bits_per_texel(format: BlockFormat) -> u32 {
    block_bytes(format) as u32 * 8 / 16
}

/// The bytes a `width` × `height` texture takes on the GPU with its full mip chain (down to 1 × 1):
/// block-compressed in `format` (whole 4 × 4 blocks per level), or RGBA8 without one (a PNG or
/// JPEG an engine uploads as it is).
pub fn gpu_bytes(width: u32, height: u32, format: Option<BlockFormat>) -> u64 {
    let (mut width, mut height) = (width.max(1) as u64, height.max(1) as u64);
    let mut bytes = 0;
    loop {
        bytes += match format {
            Some(format) => width.div_ceil(4) * height.div_ceil(4) * block_bytes(format) as u64,
            None => width * height * 4,
        };
        if width == 1 && height == 1 {
            return bytes;
        }
        (width, height) = ((width / 2).max(1), (height / 2).max(1));
    }
}

/// The bytes of one block of `format`.
pub fn block_bytes(format: BlockFormat) -> usize {
    match format {
        BlockFormat::Bc1 | BlockFormat::Bc4 => 8,
        BlockFormat::Bc3 | BlockFormat::Bc5 | BlockFormat::Bc7 => 16,
    }
}

/// What a format's blocks depend on beyond the texels and settings, for cache keys that a
/// shared cache hands between machines: the ISPC kernels' output differs between instruction-set
/// levels (`ispc::output_family`); cirrus's BC4 search gives the same bytes on every CPU.
pub fn encoder_family(format: BlockFormat) -> &'static str {
    match format {
        // 2: scored with the float palette, seeded and searched wider.
        BlockFormat::Bc4 | BlockFormat::Bc5 => "cirrus-bc4-3",
        // BC1's blocks are refined by `bc1` after the kernels; 2: scored with the float palette,
        // single-colour blocks and one-channel lines searched.
        BlockFormat::Bc1 => match super::ispc::output_family() {
            "ispc-avx2" => "ispc-avx2/bc1-2",
            "ispc-sse4" => "ispc-sse4/bc1-2",
            "ispc-sse2" => "ispc-sse2/bc1-2",
            _ => "ispc-native/bc1-2",
        },
        BlockFormat::Bc3 | BlockFormat::Bc7 => super::ispc::output_family(),
    }
}

/// Settings of one encode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct BlockEncodeSettings {
    pub format: BlockFormat,
    pub quality: EncodeQuality,
    /// Whether alpha carries data (BC7 then spends bits on it).
    pub alpha: bool,
    pub srgb: bool,
}

/// Encodes every level of a mip chain (level 0 first).
pub fn encode_levels(levels: &[Texture], settings: BlockEncodeSettings) -> EncodedTexture {
    encode_levels_hiding(levels, settings, |_| None, &never)
}

/// [`encode_levels`], the blocks `hidden_of(level)` marks at the fastest setting.
fn encode_levels_hiding<'a>(
    levels: &[Texture],
    settings: BlockEncodeSettings,
    hidden_of: impl Fn(usize) -> Option<&'a [bool]>,
    stop: ShouldStop,
) -> EncodedTexture {
    let encoded = levels
        .iter()
        .enumerate()
        .map(|(index, level)| Arc::from(encode_level_hiding(level, settings, hidden_of(index), stop)))
        .collect();
    encoded_texture(levels, settings, encoded)
}

/// The encoded texture of `levels`, hashed over its block data.
fn encoded_texture(levels: &[Texture], settings: BlockEncodeSettings, encoded: Vec<Arc<[u8]>>) -> EncodedTexture {
    EncodedTexture::from_levels(settings.format, settings.srgb, levels[0].width, levels[0].height, encoded)
}

impl EncodedTexture {
    /// An encoded texture from its block data per level (level 0 first).
    pub fn from_levels(
        format: BlockFormat,
        srgb: bool,
        width: u32,
        height: u32,
        levels: Vec<Arc<[u8]>>,
    ) -> EncodedTexture {
        let mut hasher = blake3::Hasher::new();
        for level in &levels {
            hasher.update(level);
        }
        EncodedTexture { format, srgb, width, height, levels, hash: hasher.finalize() }
    }
}

/// Blocks per parallel encoding task.
const BLOCKS_PER_TASK: usize = 1024;

/// Encodes one level; sizes that are not a multiple of 4 are padded by repeating the edge.
/// Each distinct 4×4 block is encoded once: an atlas is mostly transparent fill where many
/// blocks repeat, and a block's encoding depends on its texels only, so the result is the same
/// as encoding every block.
pub fn encode_level(level: &Texture, settings: BlockEncodeSettings) -> Vec<u8> {
    encode_level_hiding(level, settings, None, &never)
}

/// [`encode_level`], the blocks `hidden` marks (one flag per block, rows of blocks from the top)
/// at the fastest setting.
fn encode_level_hiding(
    level: &Texture,
    settings: BlockEncodeSettings,
    hidden: Option<&[bool]>,
    stop: ShouldStop,
) -> Vec<u8> {
    let channels = format_channels(settings.format);
    let texels = block_texels(level, channels);
    let blocks: Vec<&[u8]> = texels.chunks_exact(16 * channels).collect();
    encode_block_list(&blocks, (settings, hidden), stop)
}

/// The blocks of each level of a surface that no alpha test shows: where the albedo that
/// cuts the surface out (an atlas's, for its normal, height and packed surfaces) has alpha 0
/// over the block's whole footprint. They are seen only through filtering next to shown
/// texels, like the fully transparent blocks of an alpha-tested BC7 albedo, and are encoded at
/// the fastest setting: BC4/BC5 at the range's ends and grid palettes, BC1 without the
/// refinement, BC7 at the fastest profile.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HiddenBlocks {
    /// Per level (level 0 first), one flag per block, rows of blocks from the top.
    pub levels: Vec<Vec<bool>>,
    pub hash: blake3::Hash,
}

impl HiddenBlocks {
    /// The hidden blocks of a mip chain of `sizes` (level 0 first) under `albedo` (the size of
    /// level 0). A texel of a lower level is hidden when every texel its box filter reads on the
    /// level above is (a footprint of `scale` texels, widened to whole texels). None when no
    /// block is hidden or the sizes do not match. A surface stored smaller than its albedo (a
    /// level of the albedo's mip chain, see `mips::reduced_level`) starts at the albedo's level
    /// of that size.
    pub fn of_alpha(albedo: &Texture, sizes: &[(u32, u32)]) -> Option<HiddenBlocks> {
        let &first = sizes.first()?;
        let albedo_sizes = crate::mips::chain_sizes(albedo.width, albedo.height);
        let start = albedo_sizes.iter().position(|&size| size == first)?;
        let mut zero: Vec<bool> = albedo.pixels.chunks_exact(4).map(|texel| texel[3] == 0).collect();
        let (mut width, mut height) = (albedo.width as usize, albedo.height as usize);
        for &(new_width, new_height) in &albedo_sizes[1..=start] {
            let (new_width, new_height) = (new_width as usize, new_height as usize);
            zero = reduced_zeros(&zero, (width, height), (new_width, new_height));
            (width, height) = (new_width, new_height);
        }
        let mut levels = Vec::with_capacity(sizes.len());
        for (index, &(new_width, new_height)) in sizes.iter().enumerate() {
            let (new_width, new_height) = (new_width as usize, new_height as usize);
            if index > 0 {
                zero = reduced_zeros(&zero, (width, height), (new_width, new_height));
                (width, height) = (new_width, new_height);
            }
            levels.push(hidden_of_zeros(&zero, width, height));
        }
        if !levels.iter().flatten().any(|&hidden| hidden) {
            return None;
        }
        let mut hasher = blake3::Hasher::new();
        for level in &levels {
            hasher.update(&(level.len() as u64).to_le_bytes());
            hasher.update(bytemuck::cast_slice(&level.iter().map(|&hidden| hidden as u8).collect::<Vec<u8>>()));
        }
        Some(HiddenBlocks { levels, hash: hasher.finalize() })
    }
}

/// Which texels of a `to` level are zero when the `from` level's `zero` texels are, by the
/// footprints of the area-weighted box reduction between them.
fn reduced_zeros(zero: &[bool], from: (usize, usize), to: (usize, usize)) -> Vec<bool> {
    let span = |index: usize, old: usize, new: usize| {
        let start = index * old / new;
        let end = ((index + 1) * old).div_ceil(new).min(old);
        start..end.max(start + 1)
    };
    let mut reduced = vec![false; to.0 * to.1];
    for y in 0..to.1 {
        let rows = span(y, from.1, to.1);
        for x in 0..to.0 {
            let columns = span(x, from.0, to.0);
            reduced[y * to.0 + x] = rows
                .clone()
                .all(|row| zero[row * from.0 + columns.start..row * from.0 + columns.end].iter().all(|&z| z));
        }
    }
    reduced
}

/// One flag per 4×4 block: every texel of it is zero (edge blocks: the texels they have).
fn hidden_of_zeros(zero: &[bool], width: usize, height: usize) -> Vec<bool> {
    let (blocks_x, blocks_y) = (width.div_ceil(4), height.div_ceil(4));
    let mut hidden = vec![true; blocks_x * blocks_y];
    for (texel, &is_zero) in zero.iter().enumerate() {
        if !is_zero {
            hidden[(texel / width / 4) * blocks_x + texel % width / 4] = false;
        }
    }
    hidden
}

/// The bytes per texel a format's encoder reads.
fn format_channels(format: BlockFormat) -> usize {
    match format {
        BlockFormat::Bc4 => 1,
        BlockFormat::Bc5 => 2,
        _ => 4,
    }
}

/// Encodes a list of blocks (16 texels each, rows top to bottom), in order; those `hidden`
/// marks at the fastest setting.
fn encode_block_list(
    blocks: &[&[u8]],
    (settings, hidden): (BlockEncodeSettings, Option<&[bool]>),
    stop: ShouldStop,
) -> Vec<u8> {
    let channels = format_channels(settings.format);
    let block_count = blocks.len();
    // Each block's number among the distinct blocks, and the first block of each. Blocks are
    // hashed in parallel; equal hashes are confirmed byte for byte.
    let hashes: Vec<u64> = blocks.par_iter().map(|block| block_hash(block)).collect();
    let mut numbers: std::collections::HashMap<u64, u32> = std::collections::HashMap::with_capacity(block_count / 2);
    let mut distinct_of_block = Vec::with_capacity(block_count);
    let mut distinct: Vec<&[u8]> = Vec::new();
    // Whether some block of each distinct content is shown (not hidden).
    let mut shown: Vec<bool> = Vec::new();
    for (index, (&block, hash)) in blocks.iter().zip(hashes).enumerate() {
        let number = match numbers.get(&hash) {
            Some(&number) if distinct[number as usize] == block => number,
            seen => {
                distinct.push(block);
                shown.push(false);
                let number = distinct.len() as u32 - 1;
                if seen.is_none() {
                    numbers.insert(hash, number);
                }
                number
            }
        };
        shown[number as usize] |= !hidden.is_some_and(|hidden| hidden[index]);
        distinct_of_block.push(number);
    }
    // The blocks of an alpha-tested BC7 surface by what they show. Fully transparent ones are
    // seen only through filtering next to visible texels: the fastest profile. Cut-out edges
    // (some alpha below 255, not all 0): the very fast profile. With binary alpha it gave the
    // corpus trees' atlases' visible texels the same PSNR as the basic and slow ones, to a
    // hundredth of a dB, and flipped no texel across the cutoff (oak 38.74, ash 37.62, bush
    // 32.91 dB), at 3.7 times the basic one's speed. With the billboard atlases' distance-field
    // alpha ramps it keeps that: the oak's default LOD gives the same mean IoU as with the basic
    // profile (0.9477 both, 26 views) and albedo PSNR (41.19 against 41.20 dB), in 1.3 s of
    // encoding instead of 2.8 s. The others: the chosen profile.
    let alpha_profiles = settings.format == BlockFormat::Bc7 && settings.alpha;
    let mut groups: [(Vec<u32>, EncodeQuality); 3] = [
        (Vec::new(), settings.quality),
        (Vec::new(), EncodeQuality::UltraFast),
        (Vec::new(), settings.quality.min(EncodeQuality::VeryFast)),
    ];
    for (number, block) in distinct.iter().enumerate() {
        let group = match alpha_profiles.then(|| alpha_coverage(block)) {
            _ if !shown[number] => 1,
            Some(AlphaCoverage::Transparent) => 1,
            Some(AlphaCoverage::CutOut) => 2,
            _ => 0,
        };
        groups[group].0.push(number as u32);
    }
    let size = block_bytes(settings.format);
    let mut encoded = vec![0u8; distinct.len() * size];
    for (numbers, quality) in groups {
        let blocks: Vec<&[u8]> = numbers.iter().map(|&number| distinct[number as usize]).collect();
        let profile = (quality, &bc7_settings(quality, settings.alpha));
        let fresh = encode_blocks(&blocks, (settings.format, channels), profile, stop);
        for (index, &number) in numbers.iter().enumerate() {
            encoded[number as usize * size..][..size].copy_from_slice(&fresh[index * size..][..size]);
        }
    }
    let mut output = Vec::with_capacity(block_count * size);
    for &number in &distinct_of_block {
        output.extend_from_slice(&encoded[number as usize * size..][..size]);
    }
    output
}

/// What a block's alpha shows (4-channel texels).
enum AlphaCoverage {
    /// Every texel's alpha is 0.
    Transparent,
    /// Some texel's alpha below 255, not every one 0: the edge of a cut-out.
    CutOut,
    /// Anything else.
    Other,
}

fn alpha_coverage(block: &[u8]) -> AlphaCoverage {
    let (mut transparent, mut opaque) = (0, 0);
    for texel in block.chunks_exact(4) {
        match texel[3] {
            0 => transparent += 1,
            255 => opaque += 1,
            _ => {}
        }
    }
    match (transparent, opaque) {
        (16, _) => AlphaCoverage::Transparent,
        (_, 16) => AlphaCoverage::Other,
        _ => AlphaCoverage::CutOut,
    }
}

/// Encodes `blocks` (each 16 texels of `channels` bytes, rows top to bottom), in parallel; a
/// task that starts once `stop` says so encodes nothing (the caller throws the result away).
fn encode_blocks(
    blocks: &[&[u8]],
    (format, channels): (BlockFormat, usize),
    (quality, bc7_settings): (EncodeQuality, &intel_tex_2::bc7::EncodeSettings),
    stop: ShouldStop,
) -> Vec<u8> {
    let size = block_bytes(format);
    let mut encoded = vec![0u8; blocks.len() * size];
    if matches!(format, BlockFormat::Bc4 | BlockFormat::Bc5) {
        // cirrus's own BC4 search, one channel at a time (BC5: red, then green).
        let search = super::bc4::Bc4Search::for_quality(quality);
        encoded.par_chunks_mut(size).zip(blocks.par_iter()).with_min_len(64).for_each(|(output, block)| {
            if stop() {
                return;
            }
            for (channel, output) in output.chunks_exact_mut(8).enumerate() {
                let values: [u8; 16] = std::array::from_fn(|texel| block[texel * channels + channel]);
                output.copy_from_slice(&super::bc4::encode_bc4_block(&values, search));
            }
        });
        return encoded;
    }
    encoded.par_chunks_mut(size * BLOCKS_PER_TASK).zip(blocks.par_chunks(BLOCKS_PER_TASK)).for_each(
        |(output, blocks)| {
            if stop() {
                return;
            }
            // The blocks side by side: one row of blocks, 4 texels high.
            let row_len = 4 * channels;
            let stride = blocks.len() * row_len;
            let mut data = vec![0u8; stride * 4];
            for (index, block) in blocks.iter().enumerate() {
                for row in 0..4 {
                    data[row * stride + index * row_len..][..row_len]
                        .copy_from_slice(&block[row * row_len..][..row_len]);
                }
            }
            let (data, width, height, stride) = (&data[..], 4 * blocks.len() as u32, 4, stride as u32);
            match format {
                BlockFormat::Bc1 => {
                    super::ispc::compress_bc1(&intel_tex_2::RgbaSurface { data, width, height, stride }, output);
                    // Then cirrus's refinement of each block (all but the fastest settings).
                    if !matches!(quality, EncodeQuality::UltraFast | EncodeQuality::VeryFast) {
                        for (block, bytes) in blocks.iter().zip(output.chunks_exact_mut(8)) {
                            let texels: [[u8; 3]; 16] = std::array::from_fn(|texel| {
                                [block[texel * 4], block[texel * 4 + 1], block[texel * 4 + 2]]
                            });
                            let refined = super::bc1::refine_bc1_block(&texels, bytes.try_into().expect("eight bytes"));
                            bytes.copy_from_slice(&refined);
                        }
                    }
                }
                BlockFormat::Bc3 => {
                    super::ispc::compress_bc3(&intel_tex_2::RgbaSurface { data, width, height, stride }, output)
                }
                BlockFormat::Bc4 | BlockFormat::Bc5 => {
                    unreachable!("BC4 and BC5 are encoded above, by cirrus's own search")
                }
                BlockFormat::Bc7 => super::ispc::compress_bc7(
                    bc7_settings,
                    &intel_tex_2::RgbaSurface { data, width, height, stride },
                    output,
                ),
            }
        },
    );
    encoded
}

/// A 64-bit hash of a block's bytes (FxHash over 8-byte words; blocks are 16, 32 or 64 bytes).
fn block_hash(block: &[u8]) -> u64 {
    block.chunks_exact(8).fold(0u64, |hash, word| {
        (hash.rotate_left(5) ^ u64::from_le_bytes(word.try_into().expect("8 bytes")))
            .wrapping_mul(0x51_7c_c1_b7_27_22_0a_95)
    })
}

/// The first `channels` channels of every 4×4 block, block by block in row-major block order,
/// each block's rows top to bottom; texels past the level's edge repeat the last row / column.
fn block_texels(level: &Texture, channels: usize) -> Vec<u8> {
    let (blocks_x, blocks_y) = (level.width.div_ceil(4) as usize, level.height.div_ceil(4) as usize);
    let mut texels = vec![0u8; blocks_x * blocks_y * 16 * channels];
    texels.par_chunks_mut(blocks_x * 16 * channels).enumerate().for_each(|(by, block_row)| {
        for (bx, block) in block_row.chunks_exact_mut(16 * channels).enumerate() {
            copy_block(level, bx, by, channels, block);
        }
    });
    texels
}

/// Copies block (`bx`, `by`) of `level` into `block` (16 texels of `channels` bytes, rows top to
/// bottom); texels past the level's edge repeat the last row / column.
fn copy_block(level: &Texture, bx: usize, by: usize, channels: usize, block: &mut [u8]) {
    let (width, height) = (level.width as usize, level.height as usize);
    for row in 0..4 {
        let y = (by * 4 + row).min(height - 1);
        for column in 0..4 {
            let x = (bx * 4 + column).min(width - 1);
            let source = (y * width + x) * 4;
            block[(row * 4 + column) * channels..][..channels]
                .copy_from_slice(&level.pixels[source..source + channels]);
        }
    }
}

fn bc7_settings(quality: EncodeQuality, alpha: bool) -> intel_tex_2::bc7::EncodeSettings {
    use intel_tex_2::bc7;
    match (quality, alpha) {
        (EncodeQuality::UltraFast, false) => bc7::opaque_ultra_fast_settings(),
        (EncodeQuality::VeryFast, false) => bc7::opaque_very_fast_settings(),
        (EncodeQuality::Fast, false) => bc7::opaque_fast_settings(),
        (EncodeQuality::Basic, false) => bc7::opaque_basic_settings(),
        (EncodeQuality::Slow | EncodeQuality::Exhaustive, false) => bc7::opaque_slow_settings(),
        (EncodeQuality::UltraFast, true) => bc7::alpha_ultra_fast_settings(),
        (EncodeQuality::VeryFast, true) => bc7::alpha_very_fast_settings(),
        (EncodeQuality::Fast, true) => bc7::alpha_fast_settings(),
        (EncodeQuality::Basic, true) => bc7::alpha_basic_settings(),
        (EncodeQuality::Slow | EncodeQuality::Exhaustive, true) => bc7::alpha_slow_settings(),
    }
}

/// What [`encode_levels_reusing`] reuses of the surface's last encoding: the block fingerprints
/// of its level 0, its other levels' texels, and its blocks.
#[derive(Clone, Copy, Debug)]
pub struct PreviousBlocks<'a> {
    pub level0_blocks: &'a BlockFingerprints,
    pub lower_levels: &'a [Texture],
    pub encoded: &'a EncodedTexture,
}

/// Encodes a mip chain like `encode_levels`, reusing the blocks of `previous` (the same surface
/// encoded earlier with the same settings) wherever a 4×4 block's texels are unchanged: on level
/// 0 by its fingerprints (`level0_blocks`, of `levels[0]`), below by the texels. Block encoding
/// is independent per block, so the result is identical to a full encode.
pub fn encode_levels_reusing(
    levels: &[Texture],
    level0_blocks: &BlockFingerprints,
    (settings, hidden): (BlockEncodeSettings, Option<&HiddenBlocks>),
    previous: Option<PreviousBlocks>,
) -> EncodedTexture {
    encode_levels_stoppable(levels, level0_blocks, (settings, hidden), previous, &never).expect("never stops")
}

/// [`encode_levels_reusing`], asking `stop` between tasks of blocks.
pub(crate) fn encode_levels_stoppable(
    levels: &[Texture],
    level0_blocks: &BlockFingerprints,
    (settings, hidden): (BlockEncodeSettings, Option<&HiddenBlocks>),
    previous: Option<PreviousBlocks>,
    stop: ShouldStop,
) -> Result<EncodedTexture, Stopped> {
    let encoded = encode_levels_unchecked(levels, level0_blocks, (settings, hidden), previous, stop);
    if stop() {
        return Err(Stopped);
    }
    Ok(encoded)
}

fn encode_levels_unchecked(
    levels: &[Texture],
    level0_blocks: &BlockFingerprints,
    (settings, hidden): (BlockEncodeSettings, Option<&HiddenBlocks>),
    previous: Option<PreviousBlocks>,
    stop: ShouldStop,
) -> EncodedTexture {
    let hidden = hidden.filter(|hidden| {
        hidden.levels.len() == levels.len()
            && hidden.levels.iter().zip(levels).all(|(flags, level)| {
                flags.len() == level.width.div_ceil(4) as usize * level.height.div_ceil(4) as usize
            })
    });
    let hidden_of = |index: usize| hidden.map(|hidden| &hidden.levels[index][..]);
    let encode_level = |index: usize, level: &Texture| encode_level_hiding(level, settings, hidden_of(index), stop);
    let Some(previous) = previous.filter(|previous| {
        previous.encoded.format == settings.format
            && previous.encoded.srgb == settings.srgb
            && previous.lower_levels.len() + 1 == levels.len()
            && previous.encoded.levels.len() == levels.len()
    }) else {
        return encode_levels_hiding(levels, settings, hidden_of, stop);
    };
    let size = block_bytes(settings.format);
    let encoded: Vec<Arc<[u8]>> = levels
        .iter()
        .enumerate()
        .zip(&previous.encoded.levels)
        .map(|((index, level), old_blocks)| {
            let changed = if index == 0 {
                if !level0_blocks.same_size(previous.level0_blocks)
                    || (level.width, level.height) != (level0_blocks.width, level0_blocks.height)
                {
                    return Arc::from(encode_level(index, level));
                }
                let blocks_x = level0_blocks.blocks_x() as u32;
                (0..level0_blocks.texels.len())
                    .filter(|&number| level0_blocks.block_changed(previous.level0_blocks, number))
                    .map(|number| (number as u32 % blocks_x, number as u32 / blocks_x))
                    .collect::<Vec<_>>()
            } else {
                let old_level = &previous.lower_levels[index - 1];
                if (level.width, level.height) != (old_level.width, old_level.height) {
                    return Arc::from(encode_level(index, level));
                }
                if level.hash == old_level.hash {
                    return old_blocks.clone();
                }
                changed_blocks(level, old_level)
            };
            if changed.is_empty() {
                return old_blocks.clone();
            }
            if changed.len() * 2 > level.width.div_ceil(4) as usize * level.height.div_ceil(4) as usize {
                return Arc::from(encode_level(index, level));
            }
            // Only the changed blocks are gathered and encoded, then scattered.
            let channels = format_channels(settings.format);
            let mut texels = vec![0u8; changed.len() * 16 * channels];
            for (block, &(bx, by)) in texels.chunks_exact_mut(16 * channels).zip(&changed) {
                copy_block(level, bx as usize, by as usize, channels, block);
            }
            let blocks_x = level.width.div_ceil(4) as usize;
            let changed_hidden: Option<Vec<bool>> = hidden_of(index)
                .map(|hidden| changed.iter().map(|&(bx, by)| hidden[by as usize * blocks_x + bx as usize]).collect());
            let fresh = encode_block_list(
                &texels.chunks_exact(16 * channels).collect::<Vec<_>>(),
                (settings, changed_hidden.as_deref()),
                stop,
            );
            let mut blocks = old_blocks.to_vec();
            for (index, &(bx, by)) in changed.iter().enumerate() {
                let number = by as usize * blocks_x + bx as usize;
                blocks[number * size..][..size].copy_from_slice(&fresh[index * size..][..size]);
            }
            Arc::from(blocks)
        })
        .collect();
    encoded_texture(levels, settings, encoded)
}

/// The (x, y) block coordinates whose texels differ between two same-sized levels.
fn changed_blocks(level: &Texture, old: &Texture) -> Vec<(u32, u32)> {
    let (blocks_x, blocks_y) = (level.width.div_ceil(4), level.height.div_ceil(4));
    let row_bytes = level.width as usize * 4;
    let mut changed = Vec::new();
    for by in 0..blocks_y {
        for bx in 0..blocks_x {
            let x0 = bx as usize * 16;
            let x1 = ((bx as usize + 1) * 16).min(row_bytes);
            let differs = (by * 4..((by + 1) * 4).min(level.height)).any(|y| {
                let start = y as usize * row_bytes;
                level.pixels[start + x0..start + x1] != old.pixels[start + x0..start + x1]
            });
            if differs {
                changed.push((bx, by));
            }
        }
    }
    changed
}
