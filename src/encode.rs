//! Block-compressed textures: every mip level encoded to BC1/BC3/BC4/BC5/BC7 by Intel's ISPC
//! texture compressor (`intel_tex_2`), in parallel strips of block rows.

use std::fmt;
use std::sync::Arc;

use rayon::prelude::*;

use crate::config::{BlockFormat, EncodeQuality};
use crate::texture::Texture;

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
        write!(f, "EncodedTexture({:?} {}x{} ×{}, {})", self.format, self.width, self.height, self.levels.len(), &self.hash.to_hex()[..12])
    }
}

pub fn block_bytes(format: BlockFormat) -> usize {
    match format {
        BlockFormat::Bc1 | BlockFormat::Bc4 => 8,
        BlockFormat::Bc3 | BlockFormat::Bc5 | BlockFormat::Bc7 => 16,
    }
}

/// Settings of one encode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BlockEncodeSettings {
    pub format: BlockFormat,
    pub quality: EncodeQuality,
    /// Whether alpha carries data (BC7 then spends bits on it).
    pub alpha: bool,
    pub srgb: bool,
}

/// Encodes every level of a mip chain (level 0 first).
pub fn encode_levels(levels: &[Texture], settings: BlockEncodeSettings) -> EncodedTexture {
    let encoded: Vec<Arc<[u8]>> = levels.iter().map(|level| Arc::from(encode_level(level, settings))).collect();
    let mut hasher = blake3::Hasher::new();
    for level in &encoded {
        hasher.update(level);
    }
    EncodedTexture {
        format: settings.format,
        srgb: settings.srgb,
        width: levels[0].width,
        height: levels[0].height,
        levels: encoded,
        hash: hasher.finalize(),
    }
}

/// Rows of blocks per parallel task.
const BLOCK_ROWS_PER_TASK: usize = 8;

/// Encodes one level; sizes that are not a multiple of 4 are padded by repeating the edge.
pub fn encode_level(level: &Texture, settings: BlockEncodeSettings) -> Vec<u8> {
    let blocks_x = level.width.div_ceil(4) as usize;
    let blocks_y = level.height.div_ceil(4) as usize;
    let padded_width = blocks_x * 4;
    let channels = match settings.format {
        BlockFormat::Bc4 => 1,
        BlockFormat::Bc5 => 2,
        _ => 4,
    };
    let padded = padded_channels(level, padded_width, blocks_y * 4, channels);
    let row_bytes = padded_width * channels;
    let strip_bytes = row_bytes * 4 * BLOCK_ROWS_PER_TASK;
    let block_row_bytes = blocks_x * block_bytes(settings.format);
    let mut output = vec![0u8; blocks_x * blocks_y * block_bytes(settings.format)];
    let bc7_settings = bc7_settings(settings.quality, settings.alpha);
    output.par_chunks_mut(block_row_bytes * BLOCK_ROWS_PER_TASK).zip(padded.par_chunks(strip_bytes)).for_each(|(blocks, texels)| {
        let rows = texels.len() / row_bytes;
        let data = texels;
        let width = padded_width as u32;
        let height = rows as u32;
        let stride = row_bytes as u32;
        match settings.format {
            BlockFormat::Bc1 => intel_tex_2::bc1::compress_blocks_into(&intel_tex_2::RgbaSurface { data, width, height, stride }, blocks),
            BlockFormat::Bc3 => intel_tex_2::bc3::compress_blocks_into(&intel_tex_2::RgbaSurface { data, width, height, stride }, blocks),
            BlockFormat::Bc4 => intel_tex_2::bc4::compress_blocks_into(&intel_tex_2::RSurface { data, width, height, stride }, blocks),
            BlockFormat::Bc5 => intel_tex_2::bc5::compress_blocks_into(&intel_tex_2::RgSurface { data, width, height, stride }, blocks),
            BlockFormat::Bc7 => {
                intel_tex_2::bc7::compress_blocks_into(&bc7_settings, &intel_tex_2::RgbaSurface { data, width, height, stride }, blocks)
            }
        }
    });
    output
}

fn bc7_settings(quality: EncodeQuality, alpha: bool) -> intel_tex_2::bc7::EncodeSettings {
    use intel_tex_2::bc7;
    match (quality, alpha) {
        (EncodeQuality::UltraFast, false) => bc7::opaque_ultra_fast_settings(),
        (EncodeQuality::VeryFast, false) => bc7::opaque_very_fast_settings(),
        (EncodeQuality::Fast, false) => bc7::opaque_fast_settings(),
        (EncodeQuality::Basic, false) => bc7::opaque_basic_settings(),
        (EncodeQuality::Slow, false) => bc7::opaque_slow_settings(),
        (EncodeQuality::UltraFast, true) => bc7::alpha_ultra_fast_settings(),
        (EncodeQuality::VeryFast, true) => bc7::alpha_very_fast_settings(),
        (EncodeQuality::Fast, true) => bc7::alpha_fast_settings(),
        (EncodeQuality::Basic, true) => bc7::alpha_basic_settings(),
        (EncodeQuality::Slow, true) => bc7::alpha_slow_settings(),
    }
}

/// The first `channels` channels of every texel, in a `width` × `height` buffer whose extra
/// columns and rows repeat the last ones.
fn padded_channels(level: &Texture, width: usize, height: usize, channels: usize) -> Vec<u8> {
    let mut padded = Vec::with_capacity(width * height * channels);
    for y in 0..height {
        let source_y = y.min(level.height as usize - 1);
        let row = &level.pixels[source_y * level.width as usize * 4..(source_y + 1) * level.width as usize * 4];
        for x in 0..width {
            let source_x = x.min(level.width as usize - 1);
            padded.extend_from_slice(&row[source_x * 4..source_x * 4 + channels]);
        }
    }
    padded
}
