//! Compression quality: block data decoded back and compared with the uncompressed surface (PSNR
//! over the channels that carry data): BC4/BC5 and opaque BC1 with the D3D specification's float
//! palette, as a GPU decodes them (block errors in whole 35ths, and 64ths rounded), the others
//! with `bcdec_rs` (BC7's palette is integer by specification; BC3 and cut-out BC1 not yet).

use rayon::prelude::*;

use crate::encode::block_bytes;
use crate::fingerprint::BlockFingerprints;
use crate::format::BlockFormat;
use crate::Texture;

/// What an opaque BC1 surface's block errors are scaled by (float palette, rounded per block).
const BC1_ERROR_SCALE: u32 = 64;

/// PSNR reported for a lossless result (the true value is infinite).
pub(crate) const LOSSLESS_PSNR_DB: f64 = 100.0;

/// Decodes BC block data of a `width` × `height` level to RGBA8 (channels a format lacks are 0,
/// alpha 255).
pub fn decode_blocks(format: BlockFormat, blocks: &[u8], width: u32, height: u32) -> Texture {
    let blocks_x = width.div_ceil(4) as usize;
    let blocks_y = height.div_ceil(4) as usize;
    let size = block_bytes(format);
    let mut pixels = vec![0u8; (width * height * 4) as usize];
    // Block rows in parallel: each writes its own four rows of pixels.
    pixels.par_chunks_mut((width as usize * 4 * 4).max(1)).enumerate().take(blocks_y).for_each(|(by, rows)| {
        for bx in 0..blocks_x {
            let rgba = decode_block(format, &blocks[(by * blocks_x + bx) * size..][..size]);
            for row in 0..4 {
                if by * 4 + row >= height as usize {
                    break;
                }
                for column in 0..4 {
                    let x = bx * 4 + column;
                    if x >= width as usize {
                        break;
                    }
                    let target = (row * width as usize + x) * 4;
                    rows[target..target + 4].copy_from_slice(&rgba[(row * 4 + column) * 4..][..4]);
                }
            }
        }
    });
    Texture::new(width, height, pixels)
}

/// One 4×4 block decoded to RGBA8, row by row.
fn decode_block(format: BlockFormat, block: &[u8]) -> [u8; 64] {
    let mut rgba = [0u8; 64];
    match format {
        BlockFormat::Bc1 => bcdec_rs::bc1(block, &mut rgba, 16),
        BlockFormat::Bc3 => bcdec_rs::bc3(block, &mut rgba, 16),
        BlockFormat::Bc7 => bcdec_rs::bc7(block, &mut rgba, 16),
        BlockFormat::Bc4 => {
            let mut red = [0u8; 16];
            bcdec_rs::bc4(block, &mut red, 4, false);
            for (index, value) in red.iter().enumerate() {
                rgba[index * 4..index * 4 + 4].copy_from_slice(&[*value, 0, 0, 255]);
            }
        }
        BlockFormat::Bc5 => {
            let mut red_green = [0u8; 32];
            bcdec_rs::bc5(block, &mut red_green, 8, false);
            for index in 0..16 {
                rgba[index * 4..index * 4 + 4].copy_from_slice(&[
                    red_green[index * 2],
                    red_green[index * 2 + 1],
                    0,
                    255,
                ]);
            }
        }
    }
    rgba
}

/// The squared error of every 4×4 block of a level against `reference`, over its first
/// `channels` channels (texels inside the level only): what a PSNR sums, kept so that a later
/// measurement of the same surface decodes only the blocks that changed. For an alpha-tested
/// surface, also what an engine sees of each block ([`CutOutBlock`]).
#[derive(Clone, Debug, PartialEq)]
pub struct BlockErrors {
    pub format: BlockFormat,
    pub channels: usize,
    pub errors: Vec<u32>,
    /// The smallest alpha byte that passes the alpha test, and each block's [`CutOutBlock`];
    /// `None` for surfaces that are not alpha-tested.
    pub cut_out: Option<(u8, Vec<CutOutBlock>)>,
}

/// What an engine sees of one block of an alpha-tested surface: the colour where the alpha
/// test passes on the uncompressed surface, and whether the decoded alpha passes it there too.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct CutOutBlock {
    /// Squared RGB error over the texels that pass on the uncompressed surface.
    pub visible_error: u32,
    /// Texels that pass on the uncompressed surface.
    pub visible: u8,
    /// Texels that pass on the uncompressed surface or the decoded one, and on both.
    pub passing_either: u8,
    pub passing_both: u8,
    pub unused: u8,
}

/// The alpha-test figures of a surface: colour PSNR over the texels the test shows, and the
/// intersection over union of where the test passes on the uncompressed and decoded surfaces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CutOutQuality {
    pub visible_psnr_db: f64,
    pub alpha_test_iou: f64,
}

impl BlockErrors {
    /// PSNR in dB over `width` × `height` texels.
    pub fn psnr(&self, width: u32, height: u32) -> f64 {
        let squared_error: u64 = self.errors.iter().map(|&error| error as u64).sum();
        let samples = width as u64 * height as u64 * self.channels as u64;
        match self.format {
            // Errors in 35ths (see `block_errors_reusing`).
            BlockFormat::Bc4 | BlockFormat::Bc5 => {
                psnr_of_squared_error(squared_error, samples * super::bc4::BC4_ERROR_SCALE as u64)
            }
            BlockFormat::Bc1 if self.cut_out.is_none() => {
                psnr_of_squared_error(squared_error, samples * BC1_ERROR_SCALE as u64)
            }
            _ => psnr_of_squared_error(squared_error, samples),
        }
    }

    /// The alpha-test figures, for an alpha-tested surface.
    pub fn cut_out_quality(&self) -> Option<CutOutQuality> {
        let (_, blocks) = self.cut_out.as_ref()?;
        let sum = |field: fn(&CutOutBlock) -> u64| blocks.iter().map(field).sum::<u64>();
        let (error, visible) = (sum(|block| block.visible_error as u64), sum(|block| block.visible as u64));
        let (either, both) = (sum(|block| block.passing_either as u64), sum(|block| block.passing_both as u64));
        Some(CutOutQuality {
            visible_psnr_db: psnr_of_squared_error(error, visible * 3),
            alpha_test_iou: if either == 0 { 1.0 } else { both as f64 / either as f64 },
        })
    }
}

/// The smallest alpha byte that passes an alpha test at `cutoff` (as a shader tests the
/// unorm value: passing when alpha / 255 ≥ cutoff).
pub fn alpha_test_threshold(cutoff: f32) -> u8 {
    (0..=255u8).find(|&alpha| alpha as f32 / 255.0 >= cutoff).unwrap_or(255)
}

/// [`BlockErrors`] of `blocks` (BC data of `reference`'s size), reusing `previous` (the same
/// surface measured earlier: its reference's block fingerprints, its blocks and errors) for
/// every block whose data and reference texels (by `reference_blocks`, the fingerprints of
/// `reference`) are both unchanged. Equal to measuring every block.
pub fn block_errors_reusing(
    format: BlockFormat,
    blocks: &[u8],
    reference: &Texture,
    reference_blocks: &BlockFingerprints,
    measure: Measure,
    previous: Option<(&BlockFingerprints, &[u8], &BlockErrors)>,
) -> BlockErrors {
    let Measure { channels, alpha_threshold } = measure;
    let (width, height) = (reference.width as usize, reference.height as usize);
    let (blocks_x, blocks_y) = (width.div_ceil(4), height.div_ceil(4));
    let size = block_bytes(format);
    let previous = previous.filter(|(old_reference, old_blocks, old)| {
        old_reference.same_size(reference_blocks)
            && (reference_blocks.width, reference_blocks.height) == (reference.width, reference.height)
            && old_blocks.len() == blocks.len()
            && (old.format, old.channels, old.errors.len()) == (format, channels, blocks_x * blocks_y)
            && old.cut_out.as_ref().map(|(threshold, blocks)| (*threshold, blocks.len()))
                == alpha_threshold.map(|threshold| (threshold, blocks_x * blocks_y))
    });
    let mut errors = vec![(0u32, CutOutBlock::default()); blocks_x * blocks_y];
    errors.par_chunks_mut(blocks_x.max(1)).enumerate().for_each(|(by, row_errors)| {
        let rows = by * 4..(by * 4 + 4).min(height);
        for (bx, error) in row_errors.iter_mut().enumerate() {
            let number = by * blocks_x + bx;
            let block = &blocks[number * size..][..size];
            let columns = bx * 4 * 4..((bx * 4 + 4).min(width)) * 4;
            let texels = |row: usize| row * width * 4 + columns.start..row * width * 4 + columns.end;
            if let Some((old_reference, old_blocks, old)) = previous {
                let unchanged = old_blocks[number * size..][..size] == *block
                    && !reference_blocks.block_changed(old_reference, number);
                if unchanged {
                    let cut_out = old.cut_out.as_ref().map_or_else(CutOutBlock::default, |(_, blocks)| blocks[number]);
                    *error = (old.errors[number], cut_out);
                    continue;
                }
            }
            if matches!(format, BlockFormat::Bc4 | BlockFormat::Bc5) {
                // As a GPU decodes them: the float palette, in whole 35ths.
                let mut sum = 0u32;
                for channel in 0..channels {
                    // A channel the format does not hold decodes to 0.
                    let decoded = block
                        .chunks_exact(8)
                        .nth(channel)
                        .map_or([0; 16], |half| super::bc4::bc4_decode_scaled(half.try_into().expect("eight bytes")));
                    for (row_in_block, row) in rows.clone().enumerate() {
                        for (column, texel) in reference.pixels[texels(row)].chunks_exact(4).enumerate() {
                            let difference = texel[channel] as i32 * 35 - decoded[row_in_block * 4 + column];
                            sum += (difference * difference) as u32;
                        }
                    }
                }
                *error = (sum, CutOutBlock::default());
                continue;
            }
            if format == BlockFormat::Bc1 && alpha_threshold.is_none() {
                // As a GPU decodes it: the float palette, errors in 64ths (rounded per block).
                let palette = super::bc1::bc1_block_float_palette(block.try_into().expect("eight bytes"));
                let indices = u32::from_le_bytes([block[4], block[5], block[6], block[7]]);
                let mut sum = 0f64;
                for (row_in_block, row) in rows.clone().enumerate() {
                    for (column, texel) in reference.pixels[texels(row)].chunks_exact(4).enumerate() {
                        let entry = palette[(indices >> (2 * (row_in_block * 4 + column)) & 3) as usize];
                        for channel in 0..channels.min(3) {
                            sum += (texel[channel] as f64 - entry[channel] as f64).powi(2);
                        }
                    }
                }
                *error = ((sum * BC1_ERROR_SCALE as f64).round() as u32, CutOutBlock::default());
                continue;
            }
            let decoded = decode_block(format, block);
            let (mut sum, mut cut_out) = (0u32, CutOutBlock::default());
            for (row_in_block, row) in rows.clone().enumerate() {
                let source = &reference.pixels[texels(row)];
                for (column, texel) in source.chunks_exact(4).enumerate() {
                    let decoded = &decoded[(row_in_block * 4 + column) * 4..][..4];
                    for channel in 0..channels {
                        let difference = texel[channel] as i32 - decoded[channel] as i32;
                        sum += (difference * difference) as u32;
                    }
                    if let Some(threshold) = alpha_threshold {
                        let (source_passes, decoded_passes) = (texel[3] >= threshold, decoded[3] >= threshold);
                        if source_passes {
                            cut_out.visible += 1;
                            for channel in 0..3 {
                                let difference = texel[channel] as i32 - decoded[channel] as i32;
                                cut_out.visible_error += (difference * difference) as u32;
                            }
                        }
                        cut_out.passing_either += u8::from(source_passes || decoded_passes);
                        cut_out.passing_both += u8::from(source_passes && decoded_passes);
                    }
                }
            }
            *error = (sum, cut_out);
        }
    });
    let cut_out = alpha_threshold.map(|threshold| (threshold, errors.iter().map(|(_, cut_out)| *cut_out).collect()));
    BlockErrors { format, channels, errors: errors.into_iter().map(|(error, _)| error).collect(), cut_out }
}

/// What [`block_errors_reusing`] measures: the first `channels` channels, and for an
/// alpha-tested surface, the alpha byte from which the test passes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measure {
    pub channels: usize,
    pub alpha_threshold: Option<u8>,
}

/// PSNR in dB between two same-sized textures over their first `channels` channels.
pub fn psnr(reference: &Texture, decoded: &Texture, channels: usize) -> f64 {
    assert_eq!((reference.width, reference.height), (decoded.width, decoded.height), "same size");
    // Integer sums, so the parallel order does not change the result.
    let squared_error: u64 = reference
        .pixels
        .par_chunks(4 * 4096)
        .zip(decoded.pixels.par_chunks(4 * 4096))
        .map(|(reference, decoded)| {
            let mut sum = 0u64;
            for (a, b) in reference.chunks_exact(4).zip(decoded.chunks_exact(4)) {
                for channel in 0..channels {
                    let difference = a[channel] as i64 - b[channel] as i64;
                    sum += (difference * difference) as u64;
                }
            }
            sum
        })
        .sum();
    psnr_of_squared_error(squared_error, (reference.width * reference.height) as u64 * channels as u64)
}

fn psnr_of_squared_error(squared_error: u64, samples: u64) -> f64 {
    if squared_error == 0 {
        return LOSSLESS_PSNR_DB;
    }
    let mse = squared_error as f64 / samples.max(1) as f64;
    (10.0 * (255.0f64 * 255.0 / mse).log10()).min(LOSSLESS_PSNR_DB)
}

/// The levels of a KTX2, DDS or PVR texture (`path`, for messages), BC-decoded to RGBA8 with
/// the GPU's arithmetic ([`decode_blocks`]).
pub fn decoded_container_levels(
    path: &std::path::Path,
    bytes: &[u8],
) -> Result<Vec<Texture>, base::diagnostic::Diagnostic> {
    let container =
        crate::container::read_container(bytes).map_err(|error| base::diagnostic::Diagnostic::new(path, error))?;
    Ok(container
        .levels
        .iter()
        .enumerate()
        .map(|(level, blocks)| {
            let (width, height) = ((container.width >> level).max(1), (container.height >> level).max(1));
            decode_blocks(container.format, blocks, width, height)
        })
        .collect())
}
