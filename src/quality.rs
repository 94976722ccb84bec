//! Compression quality: block data decoded back with `bcdec_rs` and compared with the
//! uncompressed surface (PSNR over the channels that carry data).

use rayon::prelude::*;

use crate::config::BlockFormat;
use crate::encode::block_bytes;
use crate::texture::Texture;

/// PSNR reported for a lossless result (the true value is infinite).
pub const LOSSLESS_PSNR_DB: f64 = 100.0;

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
            let block = &blocks[(by * blocks_x + bx) * size..][..size];
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
                        rgba[index * 4..index * 4 + 4].copy_from_slice(&[red_green[index * 2], red_green[index * 2 + 1], 0, 255]);
                    }
                }
            }
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
    let samples = (reference.width * reference.height) as u64 * channels as u64;
    if squared_error == 0 {
        return LOSSLESS_PSNR_DB;
    }
    let mse = squared_error as f64 / samples as f64;
    (10.0 * (255.0f64 * 255.0 / mse).log10()).min(LOSSLESS_PSNR_DB)
}
