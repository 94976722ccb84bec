//! cirrus's BC4 encoder (`texture::bc4`, also BC5's two channels): blocks decode with `bcdec`
//! to exactly the error the search scored, and on the bundled normal maps every channel comes
//! within 0.5 dB of the windowed exhaustive optimum and beats the ISPC encoder it replaced.

use cirrus::config::EncodeQuality;
use cirrus::texture::bc4::{bc4_block_error, bc4_windowed_optimum, encode_bc4_block, Bc4Search};

/// The 4×4 blocks of one channel of an image.
fn channel_blocks(image: &image::RgbaImage, channel: usize) -> Vec<[u8; 16]> {
    let (width, height) = (image.width() as usize / 4 * 4, image.height() as usize / 4 * 4);
    let mut blocks = Vec::new();
    for by in (0..height).step_by(4) {
        for bx in (0..width).step_by(4) {
            blocks.push(std::array::from_fn(|texel| {
                image.get_pixel((bx + texel % 4) as u32, (by + texel / 4) as u32).0[channel]
            }));
        }
    }
    blocks
}

fn psnr(squared_error: f64, values: usize) -> f64 {
    10.0 * (255.0f64 * 255.0 / (squared_error / values as f64).max(1e-12)).log10()
}

/// The ISPC encoder's BC4 error over `blocks` (the encoder cirrus used before).
fn ispc_error(blocks: &[[u8; 16]]) -> f64 {
    let mut data = vec![0u8; blocks.len() * 16];
    let stride = blocks.len() * 4;
    for (index, block) in blocks.iter().enumerate() {
        for row in 0..4 {
            data[row * stride + index * 4..][..4].copy_from_slice(&block[row * 4..][..4]);
        }
    }
    let mut output = vec![0u8; blocks.len() * 8];
    let surface = intel_tex_2::RSurface { data: &data, width: stride as u32, height: 4, stride: stride as u32 };
    intel_tex_2::bc4::compress_blocks_into(&surface, &mut output);
    blocks
        .iter()
        .zip(output.chunks_exact(8))
        .map(|(block, bytes)| bc4_block_error(block, bytes.try_into().unwrap()) as f64)
        .sum()
}

#[test]
fn bc4_blocks_decode_to_the_error_the_search_scored() {
    let mut state = 99u32;
    let mut random = move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state
    };
    for case in 0..2000 {
        let (low, span) = ((random() % 256) as i32, [2, 16, 80, 255][case % 4]);
        let values: [u8; 16] =
            std::array::from_fn(|_| (low + (random() % (span + 1)) as i32 - span as i32 / 2).clamp(0, 255) as u8);
        let bytes = encode_bc4_block(&values, Bc4Search::for_quality(EncodeQuality::Basic));
        let mut decoded = [0u8; 16];
        bcdec_rs::bc4(&bytes, &mut decoded, 4, false);
        let error: u32 = values.iter().zip(decoded).map(|(&a, b)| (a as i32 - b as i32).pow(2) as u32).sum();
        assert_eq!(error, bc4_block_error(&values, &bytes), "case {case}: {values:?}");
        assert!(error >= bc4_windowed_optimum(&values, 4).min(error), "never below the optimum");
    }
}

#[test]
fn bundled_normal_maps_come_within_half_a_db_of_the_optimum() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    for map in ["examples/assets/textures/bark_birch/normal.jpg", "examples/assets/textures/bark_oak/normal.jpg"] {
        let image = image::open(root.join(map)).unwrap().into_rgba8();
        for channel in 0..2 {
            let blocks = channel_blocks(&image, channel);
            // The optimum on every 13th block (it tries every pair of a ±16 window).
            let sample: Vec<[u8; 16]> = blocks.iter().step_by(13).copied().collect();
            let optimum: f64 = sample.iter().map(|block| bc4_windowed_optimum(block, 16) as f64).sum();
            let ours: f64 = sample
                .iter()
                .map(|block| {
                    bc4_block_error(block, &encode_bc4_block(block, Bc4Search::for_quality(EncodeQuality::Basic)))
                        as f64
                })
                .sum();
            // Speed over every block of the channel, one thread.
            let clock = std::time::Instant::now();
            let encoded: Vec<[u8; 8]> = blocks
                .iter()
                .map(|block| encode_bc4_block(block, Bc4Search::for_quality(EncodeQuality::Basic)))
                .collect();
            let elapsed = clock.elapsed().as_secs_f64() * sample.len() as f64 / encoded.len() as f64;
            let values = sample.len() * 16;
            let clock = std::time::Instant::now();
            let ispc = ispc_error(&sample);
            let ispc_elapsed = clock.elapsed().as_secs_f64();
            eprintln!("ISPC {:.1} Mpix/s", values as f64 / ispc_elapsed / 1e6);
            let (ours, optimum, ispc) = (psnr(ours, values), psnr(optimum, values), psnr(ispc, values));
            eprintln!(
                "{map} channel {channel}: cirrus {ours:.2} dB, ISPC {ispc:.2} dB, optimum {optimum:.2} dB ({:.1} Mpix/s one thread)",
                values as f64 / elapsed / 1e6
            );
            assert!(ours >= optimum - 0.5, "{map} channel {channel}: {ours:.2} dB against the optimum's {optimum:.2}");
            assert!(ours > ispc, "{map} channel {channel}: {ours:.2} dB against ISPC's {ispc:.2}");
        }
    }
}

#[test]
fn bc1_refinement_never_loses_to_the_ispc_block_and_gains_on_the_bundled_bark() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let image = image::open(root.join("examples/assets/textures/bark_oak/albedo.jpg")).unwrap().into_rgba8();
    let blocks: Vec<[[u8; 3]; 16]> = (0..(image.width() / 4) * (image.height() / 4))
        .step_by(7)
        .map(|block| {
            let (bx, by) = (block % (image.width() / 4) * 4, block / (image.width() / 4) * 4);
            std::array::from_fn(|texel| {
                let pixel = image.get_pixel(bx + texel as u32 % 4, by + texel as u32 / 4).0;
                [pixel[0], pixel[1], pixel[2]]
            })
        })
        .collect();
    let (mut ispc_total, mut refined_total) = (0u64, 0u64);
    for texels in &blocks {
        let mut data = [0u8; 64];
        for (texel, rgb) in texels.iter().enumerate() {
            data[texel * 4..texel * 4 + 3].copy_from_slice(rgb);
            data[texel * 4 + 3] = 255;
        }
        let mut start = [0u8; 8];
        intel_tex_2::bc1::compress_blocks_into(
            &intel_tex_2::RgbaSurface { data: &data, width: 4, height: 4, stride: 16 },
            &mut start,
        );
        let refined = cirrus::texture::bc1::refine_bc1_block(texels, start);
        let error = |bytes: &[u8; 8]| {
            let mut decoded = [0u8; 64];
            bcdec_rs::bc1(bytes, &mut decoded, 16);
            texels
                .iter()
                .enumerate()
                .map(|(texel, rgb)| {
                    (0..3).map(|c| (rgb[c] as i64 - decoded[texel * 4 + c] as i64).pow(2) as u64).sum::<u64>()
                })
                .sum::<u64>()
        };
        let (ispc, ours) = (error(&start), error(&refined));
        assert!(ours <= ispc, "a refined block decodes worse: {ours} against {ispc}");
        (ispc_total, refined_total) = (ispc_total + ispc, refined_total + ours);
    }
    let gain = psnr(refined_total as f64, blocks.len() * 48) - psnr(ispc_total as f64, blocks.len() * 48);
    assert!(gain > 0.2, "refinement gains {gain:.2} dB");
}
