//! The ISPC encoder as the reference cirrus's block encoders are measured against, shared by the
//! `it` and `corpus` test binaries (each includes this file with `#[path]`).

/// The ISPC encoder's BC4 error over `blocks` (the encoder cirrus used before), in
/// `BC4_ERROR_SCALE` units (float palette).
pub fn ispc_bc4_error(blocks: &[[u8; 16]]) -> f64 {
    let stride = blocks.len() * 4;
    let mut data = vec![0u8; blocks.len() * 16];
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
        .map(|(block, bytes)| cirrus::texture::bc4::bc4_block_error(block, bytes.try_into().unwrap()) as f64)
        .sum()
}

/// The ISPC encoder's BC1 block of 16 opaque RGB texels (rows top to bottom).
#[allow(dead_code)] // the corpus binary measures BC4 only
pub fn ispc_bc1_block(texels: &[[u8; 3]; 16]) -> [u8; 8] {
    let mut data = [0u8; 64];
    for (texel, rgb) in texels.iter().enumerate() {
        data[texel * 4..texel * 4 + 3].copy_from_slice(rgb);
        data[texel * 4 + 3] = 255;
    }
    let mut block = [0u8; 8];
    intel_tex_2::bc1::compress_blocks_into(
        &intel_tex_2::RgbaSurface { data: &data, width: 4, height: 4, stride: 16 },
        &mut block,
    );
    block
}
